//! Gimbal protocol v2 for the virtual cameras, in-process: autopilot-link between a
//! scripted fake autopilot and a MAVLink ground station on a `udpin` endpoint, with
//! a fake vision pipeline on the bus (publishes a VisionState with two active
//! cameras, answers every VisionControl `Applied` and records it).

mod common;

use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{Mesh, PATIENCE, VEHICLE};
use mavlink::dialects::ardupilotmega::{
    GimbalManagerFlags, MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag, MavResult,
    MavState, MavType, ATTITUDE_DATA, COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA,
    GIMBAL_MANAGER_SET_ATTITUDE_DATA, GIMBAL_MANAGER_SET_PITCHYAW_DATA, HEARTBEAT_DATA,
};
use mavlink::{Connectable, Connection, MavConnection, MavHeader, TcpConfig, UdpConfig, UdpMode};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::endpoints::Bound;
use skymesh_autopilot_link::Settings;
use skymesh_ipc_types::{
    topics, AckResult, Command, ServiceId, VisionControl, VisionControlKind, VisionOrigin,
    VisionReply, VisionResult, VisionState, ZoomMode,
};
use skymesh_runtime::{Bus, Domain, Stats};

const GCS: (u8, u8) = (255, 190);
const GCS2: (u8, u8) = (250, 190);
const Q: [f32; 4] = [0.5, 0.5, -0.5, 0.5];

/// A TCP autopilot: HEARTBEAT and ATTITUDE at 5 Hz, COMMAND_LONG answered ACCEPTED,
/// every frame it receives recorded (to prove the virtual gimbals' traffic never
/// reaches it).
struct FakeAutopilot {
    port: u16,
    received: Arc<Mutex<Vec<MavMessage>>>,
    stop: Arc<AtomicBool>,
}

impl FakeAutopilot {
    fn start() -> FakeAutopilot {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let received = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (log, flag) = (received.clone(), stop.clone());
        std::thread::spawn(move || {
            let (stream, _) = listener.accept().unwrap();
            stream
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            let conn: Arc<Connection<MavMessage>> = Arc::new(
                TcpConfig::from_stream(stream)
                    .unwrap()
                    .connect::<MavMessage>()
                    .unwrap(),
            );
            let header = MavHeader {
                system_id: u32::from(VEHICLE),
                component_id: 1,
                sequence: 0,
            };
            let (c, f) = (conn.clone(), flag.clone());
            std::thread::spawn(move || {
                while !f.load(Ordering::Relaxed) {
                    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                        custom_mode: 4,
                        mavtype: MavType::MAV_TYPE_QUADROTOR,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                        system_status: MavState::MAV_STATE_STANDBY,
                        mavlink_version: 3,
                    });
                    let att = MavMessage::ATTITUDE(ATTITUDE_DATA::default());
                    if c.send(&header, &hb).is_err() || c.send(&header, &att).is_err() {
                        return;
                    }
                    std::thread::sleep(Duration::from_millis(200));
                }
            });
            while !flag.load(Ordering::Relaxed) {
                match conn.recv() {
                    Ok((_, m)) => {
                        if let MavMessage::COMMAND_LONG(c) = &m {
                            let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                                command: c.command,
                                result: MavResult::MAV_RESULT_ACCEPTED,
                                ..Default::default()
                            });
                            let _ = conn.send(&header, &ack);
                        }
                        log.lock().unwrap().push(m);
                    }
                    Err(mavlink::error::MessageReadError::Io(e))
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) => {}
                    Err(_) => return,
                }
            }
        });
        FakeAutopilot {
            port,
            received,
            stop,
        }
    }
}

impl Drop for FakeAutopilot {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The fake pipeline: its own bus node on the mesh's domain, in a thread.
struct FakePipeline {
    controls: Arc<Mutex<Vec<VisionControl>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl FakePipeline {
    fn start(domain: &Domain) -> FakePipeline {
        let controls = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (log, flag, domain) = (controls.clone(), stop.clone(), domain.clone());
        let thread = std::thread::spawn(move || {
            let bus = Bus::open(&domain, "vision-pipeline", ServiceId::Tool, 1, Stats::new())
                .expect("pipeline bus");
            let mut state_pub = bus
                .publisher::<VisionState>(&topics::vision_state())
                .unwrap();
            let control_sub = bus
                .subscriber::<VisionControl>(&topics::vision_control())
                .unwrap();
            let mut reply_pub = bus
                .publisher::<VisionReply>(&topics::vision_reply())
                .unwrap();
            let mut state = VisionState {
                stream_count: 1,
                status: 1,
                ..VisionState::default()
            };
            state.streams[0].configured = 1;
            for i in 0..2 {
                state.streams[0].cams[i].active = 1;
                state.streams[0].cams[i].ned_from_cam_q = Q;
            }
            let mut next_state = Instant::now();
            while !flag.load(Ordering::Relaxed) {
                if Instant::now() >= next_state {
                    state_pub.publish(state).unwrap();
                    next_state += Duration::from_millis(200);
                }
                while let Some(c) = control_sub.try_recv().unwrap() {
                    reply_pub
                        .publish(VisionReply {
                            request_id: c.request_id,
                            result: VisionResult::Applied.to_wire(),
                            kind: c.kind,
                            origin: c.origin,
                            ..VisionReply::default()
                        })
                        .unwrap();
                    log.lock().unwrap().push(c);
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        });
        FakePipeline {
            controls,
            stop,
            thread: Some(thread),
        }
    }

    fn take(&self) -> Vec<VisionControl> {
        std::mem::take(&mut *self.controls.lock().unwrap())
    }
}

impl Drop for FakePipeline {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A ground station on the `mavlink` crate's UDP connection. Blocking.
struct Gcs {
    conn: Connection<MavMessage>,
    header: MavHeader,
    last_heartbeat: Option<Instant>,
}

impl Gcs {
    fn open(to: SocketAddr, id: (u8, u8)) -> Gcs {
        let mut conn = UdpConfig::new(to.to_string(), UdpMode::Udpout)
            .read_timeout(Duration::from_millis(50))
            .connect::<MavMessage>()
            .expect("gcs socket");
        conn.set_protocol_version(mavlink::MavlinkVersion::V2);
        Gcs {
            conn,
            header: MavHeader {
                system_id: u32::from(id.0),
                component_id: id.1,
                sequence: 0,
            },
            last_heartbeat: None,
        }
    }

    fn send(&mut self, msg: &MavMessage) {
        self.conn.send(&self.header, msg).expect("gcs send");
        self.header.sequence = self.header.sequence.wrapping_add(1);
    }

    fn heartbeat_if_due(&mut self) {
        if self
            .last_heartbeat
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
        {
            self.last_heartbeat = Some(Instant::now());
            self.send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                mavtype: MavType::MAV_TYPE_GCS,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                ..HEARTBEAT_DATA::DEFAULT
            }));
        }
    }

    /// Receives until `f` returns `Some` (within `within`), sending heartbeats.
    fn wait_for<T>(
        &mut self,
        what: &str,
        within: Duration,
        mut f: impl FnMut(MavHeader, MavMessage) -> Option<T>,
    ) -> Option<T> {
        let deadline = Instant::now() + within;
        while Instant::now() < deadline {
            self.heartbeat_if_due();
            if let Ok((h, m)) = self.conn.recv() {
                if let Some(t) = f(h, m) {
                    return Some(t);
                }
            }
        }
        let _ = what;
        None
    }

    fn wait<T>(&mut self, what: &str, f: impl FnMut(MavHeader, MavMessage) -> Option<T>) -> T {
        self.wait_for(what, PATIENCE, f)
            .unwrap_or_else(|| panic!("gcs: no {what} within {PATIENCE:?}"))
    }

    /// Sends `msg` (a command to `component`) and waits for its COMMAND_ACK.
    fn command(&mut self, component: u8, msg: MavMessage, command: MavCmd) -> MavResult {
        self.send(&msg);
        self.wait("COMMAND_ACK", |h, m| match m {
            MavMessage::COMMAND_ACK(a) if h.component_id == component && a.command == command => {
                Some(a.result)
            }
            _ => None,
        })
    }
}

fn long(component: u8, command: MavCmd, p: [f32; 7]) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: VEHICLE,
        target_component: component,
        command,
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

fn pitchyaw(component: u8) -> MavMessage {
    long(
        component,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        [-20.0, 30.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
    )
}

async fn start(autopilot: u16, endpoints: usize) -> (Mesh, Vec<SocketAddr>) {
    let eps = vec![Endpoint::UdpIn("127.0.0.1:0".parse().unwrap()); endpoints];
    let bound = Bound::bind(&eps).await.expect("bind");
    let addrs = bound
        .local_addrs()
        .into_iter()
        .map(|a| a.unwrap())
        .collect();
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port: autopilot,
    });
    s.reconnect_max = Duration::from_secs(1);
    s.endpoints = eps;
    s.vision.enabled = true;
    s.vision.components = vec![154, 171, 172, 173];
    (Mesh::start_routed(s, Some(bound)).await, addrs)
}

/// Waits (blocking) until the pipeline recorded a control matching `pred`.
fn recorded(p: &FakePipeline, what: &str, pred: impl Fn(&VisionControl) -> bool) -> VisionControl {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(c) = p.take().into_iter().find(|c| pred(c)) {
            return c;
        }
        assert!(Instant::now() < deadline, "pipeline: no {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn virtual_cameras_are_gimbals_for_a_ground_station() {
    let ap = FakeAutopilot::start();
    let (mut mesh, addrs) = start(ap.port, 1).await;
    mesh.wait_link_up().await;
    let pipeline = FakePipeline::start(&mesh.domain);
    let to = addrs[0];
    let (pipeline, _) = tokio::task::spawn_blocking(move || {
        let mut gcs = Gcs::open(to, GCS);
        // Heartbeats from both active cameras, as gimbals.
        let mut seen = Vec::new();
        gcs.wait("heartbeats from 154 and 171", |h, m| {
            if let MavMessage::HEARTBEAT(hb) = m {
                if h.system_id == u32::from(VEHICLE) && hb.mavtype == MavType::MAV_TYPE_GIMBAL {
                    assert_ne!(h.component_id, 172, "camera 2 is not active");
                    if !seen.contains(&h.component_id) {
                        seen.push(h.component_id);
                    }
                }
            }
            (seen.len() == 2).then_some(())
        });
        gcs.wait("GIMBAL_MANAGER_STATUS", |h, m| {
            matches!(m, MavMessage::GIMBAL_MANAGER_STATUS(_) if h.component_id == 154).then_some(())
        });
        let q = gcs.wait("GIMBAL_DEVICE_ATTITUDE_STATUS", |h, m| match m {
            MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(a) if h.component_id == 171 => {
                Some((a.q, a.flags.bits()))
            }
            _ => None,
        });
        assert_eq!(q.0, Q);
        assert_ne!(q.1 & 64, 0, "YAW_IN_EARTH_FRAME");
        // Information on request.
        gcs.send(&long(
            171,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [280.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ));
        let info = gcs.wait("GIMBAL_MANAGER_INFORMATION", |h, m| match m {
            MavMessage::GIMBAL_MANAGER_INFORMATION(i) if h.component_id == 171 => Some(i),
            _ => None,
        });
        assert_eq!(info.gimbal_device_id, 171);

        // Each command: the right control, then the ack.
        let r = gcs.command(
            154,
            pitchyaw(154),
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        );
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
        let c = recorded(&pipeline, "GimbalAttitude", |c| {
            c.kind == VisionControlKind::GimbalAttitude.to_wire()
        });
        assert_eq!((c.cam, c.origin), (0, VisionOrigin::GimbalV2.to_wire()));
        assert!((c.pitch_rad + 20f32.to_radians()).abs() < 1e-5);

        let roi = MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            target_system: VEHICLE,
            target_component: 171,
            frame: MavFrame::MAV_FRAME_GLOBAL,
            command: MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            x: 473_977_420,
            y: 85_455_940,
            z: 510.0,
            ..COMMAND_INT_DATA::DEFAULT
        });
        assert_eq!(
            gcs.command(171, roi, MavCmd::MAV_CMD_DO_SET_ROI_LOCATION),
            MavResult::MAV_RESULT_ACCEPTED
        );
        let c = recorded(&pipeline, "RoiLocation", |c| {
            c.kind == VisionControlKind::RoiLocation.to_wire()
        });
        assert_eq!((c.cam, c.alt_msl_m), (1, 510.0));
        assert!((c.lat_deg - 47.397742).abs() < 1e-7);

        let none = long(171, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]);
        assert_eq!(
            gcs.command(171, none, MavCmd::MAV_CMD_DO_SET_ROI_NONE),
            MavResult::MAV_RESULT_ACCEPTED
        );
        recorded(&pipeline, "RoiNone", |c| {
            c.kind == VisionControlKind::RoiNone.to_wire() && c.cam == 1
        });

        let zoom = long(
            154,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [2.0, 60.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            gcs.command(154, zoom, MavCmd::MAV_CMD_SET_CAMERA_ZOOM),
            MavResult::MAV_RESULT_ACCEPTED
        );
        let c = recorded(&pipeline, "Zoom", |c| {
            c.kind == VisionControlKind::Zoom.to_wire()
        });
        assert_eq!((c.cam, c.zoom_mode, c.value), (0, 2, 60.0));

        // Out of range: denied without asking the pipeline.
        let bad = long(
            154,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [2.0, 160.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            gcs.command(154, bad, MavCmd::MAV_CMD_SET_CAMERA_ZOOM),
            MavResult::MAV_RESULT_DENIED
        );

        // The two gimbal-manager messages (no ack).
        gcs.send(&MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(
            GIMBAL_MANAGER_SET_PITCHYAW_DATA {
                target_system: VEHICLE,
                target_component: 171,
                flags: GimbalManagerFlags::from_bits_truncate(16),
                gimbal_device_id: 0,
                pitch: -0.25,
                yaw: 0.5,
                pitch_rate: f32::NAN,
                yaw_rate: f32::NAN,
            },
        ));
        let c = recorded(&pipeline, "SET_PITCHYAW", |c| {
            c.cam == 1 && c.yaw_rad == 0.5
        });
        assert_eq!(c.gimbal_flags, 16);
        gcs.send(&MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(
            GIMBAL_MANAGER_SET_ATTITUDE_DATA {
                target_system: VEHICLE,
                target_component: 154,
                flags: GimbalManagerFlags::from_bits_truncate(64),
                gimbal_device_id: 0,
                q: [f32::NAN; 4],
                angular_velocity_x: f32::NAN,
                angular_velocity_y: 0.1,
                angular_velocity_z: 0.2,
            },
        ));
        let c = recorded(&pipeline, "SET_ATTITUDE", |c| {
            c.cam == 0 && c.yaw_rate_rps == 0.2
        });
        assert!(c.yaw_rad.is_nan() && c.pitch_rate_rps == 0.1);

        // Take control; another ground station is then denied.
        let cfg = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
            [-2.0, -2.0, -1.0, -1.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            gcs.command(154, cfg, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE),
            MavResult::MAV_RESULT_ACCEPTED
        );
        gcs.wait("STATUS naming the primary", |h, m| match m {
            MavMessage::GIMBAL_MANAGER_STATUS(s)
                if h.component_id == 154
                    && (s.primary_control_sysid, s.primary_control_compid) == GCS =>
            {
                Some(())
            }
            _ => None,
        });
        let mut other = Gcs::open(to, GCS2);
        other.heartbeat_if_due();
        pipeline.take();
        let r = other.command(
            154,
            pitchyaw(154),
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        );
        assert_eq!(r, MavResult::MAV_RESULT_DENIED);
        assert!(
            pipeline.take().is_empty(),
            "a denied command is not sent to the pipeline"
        );
        // COMMAND_ACK carries no target here (no MAVLink 2 extensions): every peer of
        // the endpoint hears the denial; consume it before the next command.
        gcs.wait("the other station's denial", |h, m| match m {
            MavMessage::COMMAND_ACK(a) if h.component_id == 154 => {
                (a.result == MavResult::MAV_RESULT_DENIED).then_some(())
            }
            _ => None,
        });
        // The controller itself still is obeyed.
        let r = gcs.command(
            154,
            pitchyaw(154),
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        );
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
        (pipeline, ())
    })
    .await
    .unwrap();

    // Nothing addressed to a virtual camera went to the autopilot.
    let leaked: Vec<MavMessage> = ap
        .received
        .lock()
        .unwrap()
        .iter()
        .filter(|m| match m {
            MavMessage::COMMAND_LONG(c) => [154, 171].contains(&c.target_component),
            MavMessage::COMMAND_INT(c) => [154, 171].contains(&c.target_component),
            MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(_)
            | MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(_) => true,
            _ => false,
        })
        .cloned()
        .collect();
    assert!(leaked.is_empty(), "{leaked:?}");

    // A camera command of another gateway reaches the pipeline as origin Payload.
    pipeline.take();
    let ack = mesh
        .command(Command::CameraZoom {
            camera: 0,
            mode: ZoomMode::Range,
            value: 25.0,
        })
        .await;
    assert_eq!(ack.result(), Some(AckResult::Accepted), "{:?}", ack.detail);
    let c = tokio::task::spawn_blocking(move || {
        let c = recorded(&pipeline, "forwarded zoom", |c| {
            c.kind == VisionControlKind::Zoom.to_wire()
        });
        drop(pipeline);
        c
    })
    .await
    .unwrap();
    assert_eq!(c.origin, VisionOrigin::Payload.to_wire());
    assert_eq!((c.cam, c.zoom_mode, c.value), (255, 2, 25.0));
    assert!(
        mesh.metric(
            "skymesh_autopilot_gimbal_v2_total",
            "msg=pitchyaw,outcome=denied"
        ) >= 1.0
    );
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_pipeline_the_virtual_cameras_are_silent_and_commands_fail() {
    let ap = FakeAutopilot::start();
    let (mut mesh, addrs) = start(ap.port, 1).await;
    mesh.wait_link_up().await;
    let to = addrs[0];
    tokio::task::spawn_blocking(move || {
        let mut gcs = Gcs::open(to, GCS);
        // The autopilot is heard (the router works) but no virtual gimbal.
        gcs.wait("the autopilot's heartbeat", |h, m| {
            matches!(m, MavMessage::HEARTBEAT(_) if h.component_id == 1).then_some(())
        });
        let gimbal = gcs.wait_for("a virtual gimbal", Duration::from_secs(3), |h, _| {
            [154u8, 171, 172, 173]
                .contains(&h.component_id)
                .then_some(h)
        });
        assert!(gimbal.is_none(), "{gimbal:?}");
        // A command still gets its answer: FAILED after the reply timeout.
        let r = gcs.command(
            154,
            pitchyaw(154),
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        );
        assert_eq!(r, MavResult::MAV_RESULT_FAILED);
    })
    .await
    .unwrap();
    mesh.stop().await;
}
