//! Decode and encode per message for every protocol codec skymesh speaks.
//!
//! Benchmark ids are `<codec>/<decode|encode>/<message>`; throughput is the wire
//! size of the message (frame, record or JSON payload). What one iteration does:
//!
//! | codec | decode | encode |
//! |---|---|---|
//! | `solo` | `solo_proto::decode_datagram`: TLV header + `SoloMessage::decode` (what the TCP path does after the framer cut the frame) | `SoloMessage::encode` into a reused `BytesMut` |
//! | `gc` | `Record::decode` + `net_type()` (CMD_EXT_TEXT also `unpack_text`); pose: `PoseRecord::decode`, a 16-drone datagram with `pose_records` | `Record::encode` (text: `pack_text` first); pose: `encode_pose_datagram` into a reused `Vec` |
//! | `imc` | `imc_proto::decode_datagram` (header, CRC, fields, validation) | `imc_proto::encode_datagram` (a new `Vec` per datagram, as the gateway sends) |
//! | `dji` | `parse_envelope` + `parse_drc` / `parse_service` for cloud → device messages; `parse_envelope` only for device → cloud ones | cloud → device: `encode_drc_down` / `encode_service` (the fake cloud's side); device → cloud: `serde_json::to_value` of the data + `encode_drc_up` / `encode_services_reply` / `encode_event` (the gateway's side) |
//! | `digiview` | `Frame::decode` (CRC-8, header) + `Param::decode` + `Param::validate` (the gateway's handler) | `Frame::with_param` + `Frame::encode` |
//! | `mavlink_frame` | autopilot-link's `FrameParser` (`push` + `next_frame`: framing and CRC) then `RawFrame::decode` | `RawFrame::encode` |
//! | `mavlink` | the `mavlink` crate's `MavlinkReader::read_message` on an endless stream of the frame | `mavlink::write_v2_msg` into a reused `Vec` |
//!
//! `cargo bench -p skymesh-benches --bench codecs`

use std::hint::black_box;
use std::io::Read;

use bytes::BytesMut;
use criterion::measurement::WallTime;
use criterion::{criterion_group, criterion_main, BenchmarkGroup, Criterion, Throughput};

/// Registers `<group>/decode/<name>` and `<group>/encode/<name>` with the throughput
/// of `bytes` wire bytes.
fn pair<D, E>(g: &mut BenchmarkGroup<'_, WallTime>, name: &str, bytes: usize, decode: D, encode: E)
where
    D: FnMut(),
    E: FnMut(),
{
    g.throughput(Throughput::Bytes(bytes as u64));
    let (mut decode, mut encode) = (decode, encode);
    g.bench_function(format!("decode/{name}"), |b| b.iter(&mut decode));
    g.bench_function(format!("encode/{name}"), |b| b.iter(&mut encode));
}

// ---------------------------------------------------------------------------
// Solo (TLV)

fn solo(c: &mut Criterion) {
    use solo_proto::{ButtonSetting, GeofenceData, GoProState, Location, SoloMessage, SplinePoint};
    let location = Location {
        lat_deg: 37.87339177880246,
        lon_deg: -122.30124440324217,
        alt_m: 25.5,
    };
    let messages = [
        ("location", SoloMessage::Location(location)),
        ("set_current_shot", SoloMessage::SetCurrentShot(5)),
        (
            "shot_options",
            SoloMessage::ShotOptions { cruise_speed: -2.5 },
        ),
        (
            "cable_cam_options",
            SoloMessage::CableCamOptions {
                cam_interpolation: 1,
                yaw_direction_cw: 0,
                cruise_speed: -4.5,
            },
        ),
        (
            "follow_options_v2",
            SoloMessage::FollowOptionsV2 {
                cruise_speed: 3.0,
                look_at: 0,
                follow_preference: 2,
            },
        ),
        ("pause", SoloMessage::Pause),
        (
            "get_button_setting",
            SoloMessage::GetButtonSetting(ButtonSetting {
                button: 4,
                event: 0,
                shot: 1,
                mode: -1,
            }),
        ),
        (
            "spline_point",
            SoloMessage::SplinePoint(SplinePoint {
                version: 0,
                abs_alt_ref_m: 102.25,
                index: 3,
                lat_deg: -33.5,
                lon_deg: 151.25,
                alt_m: 30.0,
                pitch_deg: -45.0,
                yaw_deg: 270.0,
                u_position: 0.75,
                status: -2,
            }),
        ),
        (
            "geofence_set_data_json",
            SoloMessage::GeofenceSetData(GeofenceData {
                coord: vec![vec![
                    [37.87339177880246, -122.30124440324217],
                    [37.87342546926219, -122.30088420379124],
                    [37.87289578293214, -122.30071240112851],
                ]],
                sub_coord: vec![vec![
                    [37.87340577718139, -122.30090131123818],
                    [37.872916521332435, -122.30074261865762],
                    [37.87295869506369, -122.3012216429134],
                ]],
                kinds: vec![0],
            }),
        ),
        (
            "gopro_v2_state",
            SoloMessage::GoProV2State(GoProState {
                version: 2,
                status: 2,
                recording: 1,
                capture_mode: 1,
                video_resolution: 9,
                video_fps: 5,
                gimbal_enabled: 1,
                extra_u8: [1, 2, 3, 4, 5, 6, 7],
                extra_u16: [0x0102, 0, 0xFFFF, 7, 8],
                ..GoProState::default()
            }),
        ),
        (
            "inspect_move_vehicle",
            SoloMessage::InspectMoveVehicle {
                vx: 1.5,
                vy: -0.5,
                vz: 0.25,
            },
        ),
        (
            "shotmanager_error",
            SoloMessage::ShotManagerError("Traceback: ZeroDivisionError ✈".to_string()),
        ),
    ];
    let mut g = c.benchmark_group("solo");
    for (name, msg) in messages {
        let wire = msg.to_bytes();
        assert_eq!(
            solo_proto::decode_datagram(&wire).expect("own encoding decodes"),
            msg,
            "{name}"
        );
        let mut buf = BytesMut::with_capacity(2 * wire.len());
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                black_box(solo_proto::decode_datagram(black_box(&wire)).ok());
            },
            || {
                buf.clear();
                black_box(&msg).encode(&mut buf);
                black_box(buf.len());
            },
        );
    }
    g.finish();
}

// ---------------------------------------------------------------------------
// GroundControl (32-byte records, 84-byte pose records)

fn groundcontrol(c: &mut Criterion) {
    use gc_proto::{NetCmdType, PoseRecord, Record, RECORD_LEN};
    let records = [
        ("ping_request", Record::ping_request(7, 1500.0, 4200.0)),
        (
            "cmd_ext_waypoint",
            Record::floats(NetCmdType::CmdExtWaypoint, 3, 90, 0, [12.5, -4.0, 6.0, 2.5]),
        ),
        (
            "cmd_ext_color",
            Record::floats(NetCmdType::CmdExtColor, 3, 0, 0, [1.5, 0.0, 0.0, 0.0]),
        ),
        (
            "cmd_emergency_mode",
            Record::new(NetCmdType::CmdEmergencyMode, 0),
        ),
        (
            "ack_cmd_success",
            Record::ack(true, 3, NetCmdType::CmdExtWaypoint.id()),
        ),
        ("idle_state", Record::idle_state(2, true)),
    ];
    let mut g = c.benchmark_group("gc");
    for (name, record) in records {
        let wire = record.encode();
        assert_eq!(Record::decode(&wire), record, "{name}");
        pair(
            &mut g,
            name,
            RECORD_LEN,
            || {
                let r = Record::decode(black_box(&wire));
                black_box((r.net_type(), r));
            },
            || {
                black_box(black_box(&record).encode());
            },
        );
    }

    let text = "land at pad 3";
    let (int2, longs) = gc_proto::pack_text(text).expect("short text packs");
    let text_record = Record {
        int2,
        params: gc_proto::Params::Longs(longs),
        ..Record::new(NetCmdType::CmdExtText, 3)
    };
    let wire = text_record.encode();
    pair(
        &mut g,
        "cmd_ext_text",
        RECORD_LEN,
        || {
            let r = Record::decode(black_box(&wire));
            black_box(gc_proto::unpack_text(r.int2, r.params.as_longs()).ok());
        },
        || {
            let (int2, longs) = gc_proto::pack_text(black_box(text)).expect("packs");
            let r = Record {
                int2,
                params: gc_proto::Params::Longs(longs),
                ..Record::new(NetCmdType::CmdExtText, 3)
            };
            black_box(r.encode());
        },
    );

    let pose = |id: u16| PoseRecord {
        id,
        object_type: 0,
        liveness: 1,
        tracking: [1.0 + f32::from(id), 2.0, 10.0],
        tracking_yaw_deg: 45.0,
        target: [1.5 + f32::from(id), 2.0, 10.0],
        target_yaw_deg: 50.0,
        color: [1.0, 0.5, 0.0],
        timestamp: 12.25,
        quaternion: [0.0, 0.0, 0.38268343, 0.9238795],
        frame_count: 1234,
        drone_state: 5,
        flags: gc_proto::POSE_FLAG_ACTIVE,
        relative_rotation_deg: 0.0,
    };
    let one = pose(1);
    let one_wire = one.encode();
    pair(
        &mut g,
        "pose_record",
        gc_proto::POSE_RECORD_LEN,
        || {
            black_box(PoseRecord::decode(black_box(&one_wire)));
        },
        || {
            black_box(black_box(&one).encode());
        },
    );
    let fleet: Vec<PoseRecord> = (1..=16).map(pose).collect();
    let mut datagram = Vec::new();
    gc_proto::encode_pose_datagram(&fleet, &mut datagram);
    let mut buf = Vec::with_capacity(datagram.len());
    pair(
        &mut g,
        "pose_datagram_16_drones",
        datagram.len(),
        || {
            let records = gc_proto::pose_records(black_box(&datagram)).expect("whole records");
            for r in records {
                black_box(r);
            }
        },
        || {
            gc_proto::encode_pose_datagram(black_box(&fleet), &mut buf);
            black_box(buf.len());
        },
    );
    g.finish();
}

// ---------------------------------------------------------------------------
// IMC (UDP datagrams: 20-byte header, payload, CRC-16)

fn imc(c: &mut Criterion) {
    use imc_proto::{Announce, ChannelOp, Header, Message, SystemType, ZoomAction};
    let messages = [
        Message::Heartbeat,
        Message::Announce(Announce {
            sys_name: "skymesh-01".into(),
            sys_type: SystemType::Uav,
            owner: 0xFFFF,
            lat: 0.7188,
            lon: -0.1514,
            height: 112.5,
            services: "imc+udp://10.0.0.5:6002/;imc+info://0.0.0/".into(),
        }),
        Message::CameraZoom {
            id: 1,
            zoom: 40,
            action: ZoomAction::In,
        },
        Message::SetThrusterActuation { id: 3, value: -0.5 },
        Message::SetServoPosition {
            id: 9,
            value: std::f32::consts::FRAC_PI_2,
        },
        Message::SetControlSurfaceDeflection { id: 2, angle: 4.0 },
        Message::RemoteActions {
            actions: "Propulsion=0.6;Lights=1".into(),
        },
        Message::ButtonEvent {
            button: 4,
            value: 1,
        },
        Message::PowerChannelControl {
            name: "camera".into(),
            op: ChannelOp::Restart,
            sched_time: 0.0,
        },
        Message::SetLedBrightness {
            name: "strobe".into(),
            value: 128,
        },
        Message::SetPwm {
            id: 7,
            period: 20_000,
            duty_cycle: 1_500,
        },
        Message::GpioStateSet {
            name: "payload_en".into(),
            value: 1,
        },
    ];
    let header = Header::new(1.5, 0x4001, 5, 0x2000, 255);
    let mut g = c.benchmark_group("imc");
    for msg in messages {
        let name = msg.name();
        let wire = imc_proto::encode_datagram(&header, &msg).expect("encodes");
        let back = imc_proto::decode_datagram(&wire).expect("own encoding decodes");
        assert_eq!(back.message, msg, "{name}");
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                black_box(imc_proto::decode_datagram(black_box(&wire)).ok());
            },
            || {
                black_box(imc_proto::encode_datagram(black_box(&header), black_box(&msg)).ok());
            },
        );
    }
    g.finish();
}

// ---------------------------------------------------------------------------
// DJI Cloud API (JSON over MQTT)

const DJI_TAKEOFF_TO_POINT: &str = r#"{"bid":"2b0b9a5c-6a1c-4c39-9a8e-4a0f0b5d1c21","method":"takeoff_to_point","data":{"commander_flight_height":80,"commander_mode_lost_action":1,"flight_id":"ABDEAC21DCADDA","max_speed":12,"rc_lost_action":0,"rth_altitude":100,"security_takeoff_height":100,"target_height":100,"target_latitude":12.23,"target_longitude":12.32},"tid":"6a7bfe89-c386-4043-b600-b518e10096cc","timestamp":1654070968655}"#;
const DJI_FLY_TO_POINT: &str = r#"{"bid":"2b0b9a5c-6a1c-4c39-9a8e-4a0f0b5d1c21","method":"fly_to_point","data":{"fly_to_id":"b5d2c8e0-6f0e-4d0a-9a55-3b0e6d2f1a77","max_speed":12,"points":[{"height":100,"latitude":12.23,"longitude":12.23}]},"tid":"6a7bfe89-c386-4043-b600-b518e10096cc","timestamp":1654070968655}"#;
const DJI_AUTHORITY_GRAB: &str = r#"{"bid":"2b0b9a5c-6a1c-4c39-9a8e-4a0f0b5d1c21","method":"flight_authority_grab","data":{},"tid":"6a7bfe89-c386-4043-b600-b518e10096cc","timestamp":1654070968655}"#;

fn dji(c: &mut Criterion) {
    use dji_proto::{
        encode_drc_down, encode_drc_up, encode_event, encode_service, encode_services_reply,
        parse_drc, parse_envelope, parse_service, DrcDown, DroneControl, FlyToPointProgress,
        HeartBeatEcho, OsdInfoPush, PathPoint, TaskStatus, TopicKind,
    };
    const SN: &str = "4TADKAQ000002J";
    const NOW_MS: u64 = 1_670_415_891_013;
    let mut g = c.benchmark_group("dji");

    // Cloud → device, drc/down: the stick stream and its heartbeat.
    let drc = [
        (
            "drone_control",
            DrcDown::DroneControl(DroneControl {
                seq: 1,
                x: 2.34,
                y: -2.45,
                h: 2.76,
                w: 2.86,
            }),
        ),
        (
            "heart_beat",
            DrcDown::HeartBeat {
                seq: 10,
                timestamp: 1_670_415_891_013,
            },
        ),
    ];
    for (name, msg) in drc {
        let wire = encode_drc_down(&msg);
        let env = parse_envelope(TopicKind::DrcDown, &wire).expect("envelope");
        assert_eq!(parse_drc(&env).expect("valid"), msg, "{name}");
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                let env = parse_envelope(TopicKind::DrcDown, black_box(&wire)).ok();
                black_box(env.map(|e| parse_drc(&e)));
            },
            || {
                black_box(encode_drc_down(black_box(&msg)));
            },
        );
    }

    // Cloud → device, services.
    for (name, text) in [
        ("fly_to_point", DJI_FLY_TO_POINT),
        ("takeoff_to_point", DJI_TAKEOFF_TO_POINT),
        ("flight_authority_grab", DJI_AUTHORITY_GRAB),
    ] {
        let wire = text.as_bytes();
        let env = parse_envelope(TopicKind::Services, wire).expect("envelope");
        let request = parse_service(&env).expect("valid request");
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                let env = parse_envelope(TopicKind::Services, black_box(wire)).ok();
                black_box(env.map(|e| parse_service(&e)));
            },
            || {
                black_box(encode_service(
                    black_box(&request),
                    &env.tid,
                    &env.bid,
                    NOW_MS,
                ));
            },
        );
    }

    // Device → cloud: the gateway's encoders; decode is the envelope only (no typed
    // parser exists for the device's own messages).
    let osd = OsdInfoPush {
        attitude_head: 60.0,
        latitude: 22.579_682,
        longitude: 113.938_37,
        height: 120.5,
        speed_x: 1.5,
        speed_y: -0.25,
        speed_z: 0.1,
        gimbal_pitch: -30.0,
        gimbal_roll: 0.0,
        gimbal_yaw: 60.0,
    };
    let osd_wire = encode_drc_up(
        "osd_info_push",
        serde_json::to_value(osd).expect("serialises"),
        None,
        NOW_MS,
    );
    pair(
        &mut g,
        "osd_info_push",
        osd_wire.len(),
        || {
            black_box(parse_envelope(TopicKind::DrcUp, black_box(&osd_wire)).ok());
        },
        || {
            let data = serde_json::to_value(black_box(osd)).expect("serialises");
            black_box(encode_drc_up("osd_info_push", data, None, NOW_MS));
        },
    );
    let echo = HeartBeatEcho {
        seq: 10,
        timestamp: 1_670_415_891_013,
    };
    let echo_wire = encode_drc_up(
        "heart_beat",
        serde_json::to_value(echo).expect("serialises"),
        None,
        NOW_MS,
    );
    pair(
        &mut g,
        "heart_beat_echo",
        echo_wire.len(),
        || {
            black_box(parse_envelope(TopicKind::DrcUp, black_box(&echo_wire)).ok());
        },
        || {
            let data = serde_json::to_value(black_box(echo)).expect("serialises");
            black_box(encode_drc_up("heart_beat", data, None, NOW_MS));
        },
    );
    let request = parse_envelope(TopicKind::Services, DJI_FLY_TO_POINT.as_bytes()).expect("ok");
    let reply_wire = encode_services_reply(&request, SN, 0, None, NOW_MS);
    pair(
        &mut g,
        "services_reply",
        reply_wire.len(),
        || {
            black_box(parse_envelope(TopicKind::ServicesReply, black_box(&reply_wire)).ok());
        },
        || {
            black_box(encode_services_reply(
                black_box(&request),
                SN,
                0,
                None,
                NOW_MS,
            ));
        },
    );
    let progress = FlyToPointProgress {
        fly_to_id: "b5d2c8e0-6f0e-4d0a-9a55-3b0e6d2f1a77".into(),
        status: TaskStatus::WaylineProgress,
        result: 0,
        way_point_index: 0,
        remaining_distance: 125.4,
        remaining_time: 10.5,
        planned_path_points: vec![PathPoint {
            latitude: 12.23,
            longitude: 12.23,
            height: 100.0,
        }],
    };
    let tid = "6a7bfe89-c386-4043-b600-b518e10096cc";
    let bid = "2b0b9a5c-6a1c-4c39-9a8e-4a0f0b5d1c21";
    let event_wire = encode_event(
        SN,
        "fly_to_point_progress",
        serde_json::to_value(&progress).expect("serialises"),
        false,
        tid,
        bid,
        NOW_MS,
    );
    pair(
        &mut g,
        "fly_to_point_progress",
        event_wire.len(),
        || {
            black_box(parse_envelope(TopicKind::Events, black_box(&event_wire)).ok());
        },
        || {
            let data = serde_json::to_value(black_box(&progress)).expect("serialises");
            black_box(encode_event(
                SN,
                "fly_to_point_progress",
                data,
                false,
                tid,
                bid,
                NOW_MS,
            ));
        },
    );
    g.finish();
}

// ---------------------------------------------------------------------------
// DigiView (88-byte frames)

fn digiview(c: &mut Criterion) {
    use digiview_proto::{
        BoundingBox, CamOpticsAndControl, CamTargeting, Capture, DetectedRoi, Frame, MessageType,
        Param, SingleTargetTracking, StreamName, SystemStatus, VideoOutput, FRAME_LEN,
    };
    let stream = |s: &str| StreamName::new(s).expect("short name");
    let params = [
        (
            "set_cam_targeting",
            MessageType::Set,
            Param::CamTargeting(CamTargeting {
                stream: stream("cam0"),
                cam: 1,
                mode: 0,
                euler_delta: true,
                yaw: 1.571,
                pitch: -0.5,
                roll: 0.0,
                lock_flags: 3,
                x_offset: 16384.0 / 32767.0,
                y_offset: -1.0,
                latitude: 59.329,
                longitude: 18.068,
                altitude: 120.5,
            }),
        ),
        (
            "set_cam_optics_and_control",
            MessageType::Set,
            Param::CamOpticsAndControl(CamOpticsAndControl {
                stream: stream("cam0"),
                cam: 1,
                zoom: 4,
                fov: 0.5,
                crop_mode: 0,
            }),
        ),
        (
            "set_single_target_tracking",
            MessageType::Set,
            Param::SingleTargetTracking(SingleTargetTracking {
                command: 1,
                stream: stream("main"),
                cam: 0,
                x_offset: 0.25,
                y_offset: -0.125,
                detection_id: 3,
                zoom: 2,
                confidence: 0.75,
                yaw_global: 0.5,
                pitch_global: -0.25,
                rel_frame: 0,
                yaw_rel: 0.5,
                pitch_rel: -0.25,
            }),
        ),
        (
            "set_capture",
            MessageType::Set,
            Param::Capture(Capture {
                stream: stream("main"),
                single_image: true,
                record_video: false,
                images_captured: 0,
                videos_captured: 0,
            }),
        ),
        (
            "current_detected_roi",
            MessageType::Current,
            Param::DetectedRoi(DetectedRoi {
                index: 2,
                score: 200,
                total: 5,
                object_type: 3,
                yaw_global: -3.0,
                pitch_global: -0.25,
                rel_frame: 2,
                yaw_rel: 0.1,
                pitch_rel: 0.05,
                latitude: 1.0,
                longitude: -1.0,
                altitude: 50.0,
                distance: 70.711,
            }),
        ),
        (
            "current_video_output",
            MessageType::Current,
            Param::VideoOutput(VideoOutput {
                stream: stream("main"),
                width: 1920,
                height: 1080,
                fps: 30,
                layout_mode: 2,
                layout_views: 2,
                overlay_mode: 2,
                views: vec![
                    BoundingBox {
                        x: 0,
                        y: 0,
                        w: 850,
                        h: 1080,
                    },
                    BoundingBox {
                        x: 850,
                        y: 0,
                        w: 850,
                        h: 1080,
                    },
                ],
                overlay_box: BoundingBox {
                    x: 1700,
                    y: 0,
                    w: 220,
                    h: 1080,
                },
                single_detection_size: 220,
            }),
        ),
        (
            "current_system_status",
            MessageType::Current,
            Param::SystemStatus(SystemStatus {
                status: 1,
                error: 0,
                temperature: 45.5,
            }),
        ),
    ];
    let mut g = c.benchmark_group("digiview");
    for (name, message_type, param) in params {
        let frame = Frame {
            timestamp: 0x0102_0304_0506_0708,
            ..Frame::with_param(message_type, &param)
        };
        let wire = frame.encode();
        let back = Frame::decode(&wire).expect("own encoding decodes");
        let p = Param::decode(back.param_type, &back.data).expect("payload decodes");
        p.validate()
            .unwrap_or_else(|e| panic!("{name}: out of range: {e}"));
        // Fixed-point fields round; the payload must survive a second trip unchanged.
        assert_eq!(p.encode().1, back.data, "{name}");
        pair(
            &mut g,
            name,
            FRAME_LEN,
            || {
                let checked = Frame::decode(black_box(&wire)).ok().map(|f| {
                    Param::decode(f.param_type, &f.data).and_then(|p| p.validate().map(|()| p))
                });
                black_box(checked);
            },
            || {
                let f = Frame {
                    timestamp: 0x0102_0304_0506_0708,
                    ..Frame::with_param(message_type, black_box(&param))
                };
                black_box(f.encode());
            },
        );
    }
    g.finish();
}

// ---------------------------------------------------------------------------
// MAVLink 2 (autopilot-link's framing, the `mavlink` crate)

/// An endless byte stream repeating one frame (a serial port that never stops).
struct Repeat<'a> {
    frame: &'a [u8],
    at: usize,
}

impl Read for Repeat<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut n = 0;
        while n < buf.len() {
            let take = (self.frame.len() - self.at).min(buf.len() - n);
            buf[n..n + take].copy_from_slice(&self.frame[self.at..self.at + take]);
            n += take;
            self.at = (self.at + take) % self.frame.len();
        }
        Ok(n)
    }
}

fn mavlink_messages() -> Vec<(&'static str, mavlink::dialects::ardupilotmega::MavMessage)> {
    use mavlink::dialects::ardupilotmega::{
        MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag, MavState, MavType,
        PositionTargetTypemask, ATTITUDE_DATA, COMMAND_LONG_DATA, GLOBAL_POSITION_INT_DATA,
        HEARTBEAT_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
    };
    vec![
        (
            "heartbeat",
            MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 4,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }),
        ),
        (
            "attitude",
            MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: 123_456,
                roll: 0.05,
                pitch: -0.02,
                yaw: 1.2,
                rollspeed: 0.01,
                pitchspeed: -0.01,
                yawspeed: 0.1,
            }),
        ),
        (
            "global_position_int",
            MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms: 123_456,
                lat: -353_632_610,
                lon: 1_491_652_300,
                alt: 594_000,
                relative_alt: 10_000,
                vx: 200,
                vy: -10,
                vz: 5,
                hdg: 9_000,
            }),
        ),
        (
            "set_position_target_local_ned",
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
                vx: 5.0,
                vy: 0.5,
                vz: -0.25,
                yaw_rate: 0.17,
                type_mask: PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
                    | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE,
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
                ..Default::default()
            }),
        ),
        (
            "command_long",
            MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: 1.0,
                command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                target_system: 1,
                target_component: 1,
                ..Default::default()
            }),
        ),
    ]
}

fn mavlink_header() -> mavlink::MavHeader {
    mavlink::MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: 7,
    }
}

fn mavlink_frame(c: &mut Criterion) {
    use mavlink_frame::{FrameParser, RawFrame};
    let mut g = c.benchmark_group("mavlink_frame");
    let mut parser = FrameParser::new();
    for (name, msg) in mavlink_messages() {
        let frame = RawFrame::encode(mavlink_header(), &msg);
        let wire = frame.as_bytes().to_vec();
        parser.push(&wire);
        let parsed = parser.next_frame().expect("one whole frame");
        assert_eq!(parsed.decode().expect("decodes"), msg, "{name}");
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                parser.push(black_box(&wire));
                let f = parser.next_frame().expect("one whole frame");
                black_box(f.decode().ok());
            },
            || {
                black_box(RawFrame::encode(mavlink_header(), black_box(&msg)));
            },
        );
    }
    g.finish();
}

fn mavlink_crate(c: &mut Criterion) {
    use mavlink::dialects::ardupilotmega::MavMessage;
    use mavlink::{MavlinkReader, MavlinkVersion};
    let mut g = c.benchmark_group("mavlink");
    for (name, msg) in mavlink_messages()
        .into_iter()
        .filter(|(n, _)| matches!(*n, "set_position_target_local_ned" | "attitude"))
    {
        let mut wire = Vec::new();
        mavlink::write_v2_msg(&mut wire, mavlink_header(), &msg).expect("writes");
        let mut reader = MavlinkReader::new(Repeat {
            frame: &wire,
            at: 0,
        });
        let (_, first) = reader
            .read_message::<MavMessage>(MavlinkVersion::V2)
            .expect("parses");
        assert_eq!(first, msg, "{name}");
        let mut out = Vec::with_capacity(2 * wire.len());
        pair(
            &mut g,
            name,
            wire.len(),
            || {
                black_box(reader.read_message::<MavMessage>(MavlinkVersion::V2).ok());
            },
            || {
                out.clear();
                black_box(mavlink::write_v2_msg(&mut out, mavlink_header(), black_box(&msg)).ok());
            },
        );
    }
    g.finish();
}

criterion_group!(
    benches,
    solo,
    groundcontrol,
    imc,
    dji,
    digiview,
    mavlink_frame,
    mavlink_crate
);
criterion_main!(benches);
