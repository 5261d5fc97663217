//! The in-process harness: digiview-gateway on loopback port 0 in its own iceoryx2
//! domain, a FAKE PIPELINE task on a tool node (publishes a known `VisionState`,
//! answers every `ViewControl` with a chosen result and records it; a
//! `DirectionAt` is answered with [`fake_direction`]), and a raw TCP DigiView
//! client built on the same codec.
#![allow(dead_code)] // each test crate uses its own subset

use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::BytesMut;
use digiview_proto::{Frame, FrameCodec, MessageType, Param, ParamType, RawFrame};
use skymesh_digiview_gateway::{bind, run, Settings};
use skymesh_ipc_types::{
    topics, view, FixedStr, ServiceId, ViewControl, ViewControlKind, ViewReply, VirtualCamState,
    VisionDetection, VisionResult, VisionState,
};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Stats};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::codec::Decoder;

/// Generous bound for anything that should take a moment (never a timing claim).
pub const PATIENCE: Duration = Duration::from_secs(20);

fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "dvgw{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// The state the fake pipeline publishes: one stream `main` (layout 4, four views),
/// two models, three detections (overlay slots 0, none, 1; the first geolocated).
pub fn known_state() -> VisionState {
    let mut s = VisionState {
        status: 1,
        ai_enabled: 1,
        model_count: 2,
        stream_count: 1,
        detection_count: 3,
        temperature_valid: 1,
        detection_mode: 7,
        sorting_mode: 1,
        temperature_c: 48.5,
        track_confidence: 0.5,
        scan_confidence: 0.25,
        track_overlap: 0.3,
        scan_overlap: 0.6,
        creation_score: 10,
        bonus_detection: 20,
        bonus_redetection: 30,
        missed_detection_penalty: 40,
        missed_redetection_penalty: 50,
        track_model: FixedStr::new("people"),
        scan_model: FixedStr::new("blobs"),
        ..VisionState::default()
    };
    s.models[0] = FixedStr::new("blobs");
    s.models[1] = FixedStr::new("people");
    let st = &mut s.streams[0];
    st.name = FixedStr::new("main");
    st.configured = 1;
    st.receiving = 1;
    st.layout_mode = 4;
    st.overlay_mode = 2;
    st.num_views = 4;
    st.recording = 1;
    st.out_width = 1280;
    st.out_height = 720;
    st.overlay_box = [1160, 0, 120, 720];
    st.single_detection_size = 120;
    st.images_captured = 3;
    st.videos_captured = 1;
    st.vehicle_heading_rad = 0.5;
    for (i, c) in st.cams.iter_mut().enumerate() {
        let f = i as f32;
        *c = VirtualCamState {
            targeting_mode: (i % 4) as u8,
            euler_delta: 0,
            lock_flags: 0b011,
            crop_mode: 1,
            zoom: 10 * i as i8 - 5,
            active: 1,
            detection_id: 255,
            aim_valid: 1,
            yaw_rad: 0.25 * f - 0.5,
            pitch_rad: -0.2 - 0.1 * f,
            roll_rad: 0.0,
            x_offset: 0.1 * f,
            y_offset: -0.05 * f,
            fov_rad: 1.0 + 0.1 * f,
            effective_hfov_rad: 0.9,
            target_alt_rel_m: -30.0,
            target_lat_deg: 58.4 + f64::from(f),
            target_lon_deg: 15.6,
            // Camera axis north, level: camera x → NED x (identity).
            ned_from_cam_q: [1.0, 0.0, 0.0, 0.0],
            view_yaw_rad: 0.0,
            view_pitch_rad: 0.0,
            view_rect: [(i as u16 % 2) * 580, (i as u16 / 2) * 360, 580, 360],
        };
    }
    st.stt.mode = 2;
    st.stt.cam = 1;
    st.stt.detection_id = 4;
    st.stt.locked = 1;
    st.stt.rel_frame = 1;
    st.stt.zoom_level = 3;
    st.stt.confidence = 0.75;
    st.stt.yaw_global_rad = 1.0;
    st.stt.pitch_global_rad = -0.3;
    st.stt.yaw_heading_rad = 0.5;
    st.stt.pitch_heading_rad = -0.3;
    st.stt.yaw_camera_rad = 0.1;
    st.stt.pitch_camera_rad = 0.05;
    for (i, d) in s.detections.iter_mut().take(3).enumerate() {
        let f = i as f32;
        *d = VisionDetection {
            id: 10 + i as u8,
            score: 200 - 50 * i as u8,
            stream: 0,
            overlay_slot: [0, 255, 1][i],
            geo_valid: u8::from(i == 0),
            model: 0,
            object_type: i as i16,
            age_frames: 5,
            confidence: 0.9,
            bbox: [10, 10, 20, 20],
            yaw_global_rad: 0.2 + f,
            pitch_global_rad: -0.4,
            yaw_heading_rad: -0.3 + f,
            pitch_heading_rad: -0.4,
            yaw_camera_rad: 0.05 * f,
            pitch_camera_rad: -0.02,
            lat_deg: 58.41,
            lon_deg: 15.62,
            alt_msl_m: 120.5,
            distance_m: 85.25,
        };
    }
    s
}

/// The fake pipeline's direction at offset (x, y) of any view: global yaw/pitch,
/// then relative to the camera's axis (radians).
pub fn fake_direction(x: f64, y: f64) -> [f64; 4] {
    [0.5 + x, -0.25 + y / 2.0, x / 2.0, y / 4.0]
}

/// How the fake pipeline answers: a result and message, or silence.
pub type Answer = Option<(VisionResult, &'static str)>;

/// digiview-gateway running in-process, and the fake pipeline.
pub struct Gateway {
    pub domain: Domain,
    pub stats: Stats,
    pub tcp: SocketAddr,
    /// Every `ViewControl` the fake pipeline received.
    pub controls: mpsc::UnboundedReceiver<ViewControl>,
    /// How the fake pipeline answers the next controls.
    pub answer: Arc<Mutex<Answer>>,
    /// The state it publishes (every 100 ms).
    pub state: Arc<Mutex<Option<VisionState>>>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
    pipeline: Option<JoinHandle<()>>,
}

impl Gateway {
    pub async fn start() -> Gateway {
        Gateway::start_with(|_| {}).await
    }

    /// Starts with the loopback defaults changed by `adjust`.
    pub async fn start_with(adjust: impl FnOnce(&mut Settings)) -> Gateway {
        let mut settings = Settings::loopback_any_port();
        adjust(&mut settings);
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "digiview-gateway",
            ServiceId::DigiviewGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
        let tool = Bus::open(&domain, "pipeline-fake", ServiceId::Tool, 0, Stats::new())
            .expect("tool bus");
        let mut control_sub = tool
            .subscriber::<ViewControl>(&view::view_control())
            .expect("view_control subscriber");
        let mut reply_pub = tool
            .publisher::<ViewReply>(&view::view_reply())
            .expect("view_reply publisher");
        let mut state_pub = tool
            .publisher::<VisionState>(&topics::vision_state())
            .expect("vision_state publisher");
        let (controls_tx, controls) = mpsc::unbounded_channel();
        let answer: Arc<Mutex<Answer>> = Arc::new(Mutex::new(Some((VisionResult::Applied, ""))));
        let state = Arc::new(Mutex::new(Some(known_state())));
        let shutdown = CancellationToken::new();
        let pipeline = {
            let (answer, state, stop) = (answer.clone(), state.clone(), shutdown.clone());
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_millis(100));
                loop {
                    tokio::select! {
                        _ = stop.cancelled() => return,
                        _ = tick.tick() => {
                            let s = *state.lock().unwrap();
                            if let Some(s) = s {
                                state_pub.publish(s).expect("publish state");
                            }
                        }
                        c = control_sub.recv() => {
                            let c = c.expect("view_control");
                            let a = *answer.lock().unwrap();
                            if let Some((result, message)) = a {
                                let [yg, pg, yc, pc] = if c.kind() == Ok(ViewControlKind::DirectionAt) {
                                    fake_direction(c.x_offset, c.y_offset)
                                } else {
                                    [0.0; 4]
                                };
                                reply_pub.publish(ViewReply {
                                    request_id: c.request_id,
                                    result: result.to_wire(),
                                    kind: c.kind,
                                    origin: c.origin,
                                    yaw_global_rad: yg,
                                    pitch_global_rad: pg,
                                    yaw_camera_rad: yc,
                                    pitch_camera_rad: pc,
                                    message: FixedStr::new(message),
                                    ..ViewReply::default()
                                }).expect("publish reply");
                            }
                            let _ = controls_tx.send(c);
                        }
                    }
                }
            })
        };
        let listener = bind(&settings).await.expect("bind");
        let tcp = listener.local_addr().expect("address");
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "digiview-gateway");
        let task = tokio::spawn(run(settings, listener, ctx));
        let gw = Gateway {
            domain,
            stats,
            tcp,
            controls,
            answer,
            state,
            shutdown,
            task: Some(task),
            pipeline: Some(pipeline),
        };
        // Wait until the gateway has a state, so the first GET is not "pipeline down".
        let mut c = gw.client().await;
        let deadline = Instant::now() + PATIENCE;
        loop {
            c.send(&Frame::new(MessageType::Get, ParamType::SystemStatus))
                .await;
            let r = c.recv().await;
            if r.message_type == MessageType::Current as u8 {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the gateway never saw a VisionState"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        gw
    }

    pub async fn client(&self) -> Client {
        Client::connect(self.tcp, None).await
    }

    /// Sets how the fake pipeline answers.
    pub fn answer_with(&self, a: Answer) {
        *self.answer.lock().unwrap() = a;
    }

    pub fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }

    /// Waits until the series reaches `value`.
    pub async fn wait_metric(&self, name: &str, labels: &str, value: f64) {
        let deadline = Instant::now() + PATIENCE;
        while self.metric(name, labels) != Some(value) {
            assert!(
                Instant::now() < deadline,
                "{name}{{{labels}}} is {:?}, expected {value}",
                self.metric(name, labels)
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// The next control the fake pipeline received.
    pub async fn next_control(&mut self) -> ViewControl {
        tokio::time::timeout(PATIENCE, self.controls.recv())
            .await
            .expect("a ViewControl within patience")
            .expect("pipeline task alive")
    }

    /// Stops the gateway (it must return `Ok` promptly) and cleans the domain.
    pub async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            tokio::time::timeout(Duration::from_secs(5), task)
                .await
                .expect("digiview-gateway stops within 5 s")
                .expect("digiview-gateway task")
                .expect("digiview-gateway result");
        }
        if let Some(p) = self.pipeline.take() {
            let _ = p.await;
        }
        self.domain.remove_leftover_files();
    }
}

/// A raw DigiView client.
pub struct Client {
    stream: TcpStream,
    buf: BytesMut,
}

impl Client {
    pub async fn connect(addr: SocketAddr, from: Option<IpAddr>) -> Client {
        let stream = skymesh_runtime::net::connect_tcp(addr, from)
            .await
            .expect("connect");
        Client {
            stream,
            buf: BytesMut::new(),
        }
    }

    pub async fn send(&mut self, f: &Frame) {
        self.send_raw(&f.encode()).await;
    }

    pub async fn send_raw(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).await.expect("send");
    }

    /// The next frame within `timeout` (checksum checked), `None` on timeout or
    /// close.
    pub async fn recv_within(&mut self, timeout: Duration) -> Option<RawFrame> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Ok(Some(item)) = FrameCodec::new().decode(&mut self.buf) {
                let raw = match item {
                    Ok(f) => RawFrame::parse(&f.encode()),
                    Err(bad) => bad.raw,
                };
                assert_eq!(raw.checksum, raw.computed_checksum(), "reply checksum");
                return Some(raw);
            }
            match tokio::time::timeout_at(deadline, self.stream.read_buf(&mut self.buf)).await {
                Err(_) | Ok(Ok(0)) | Ok(Err(_)) => return None,
                Ok(Ok(_)) => {}
            }
        }
    }

    /// The next frame; panics if none comes within patience.
    pub async fn recv(&mut self) -> RawFrame {
        self.recv_within(PATIENCE)
            .await
            .expect("a reply within patience")
    }

    /// Asserts nothing arrives within `window`.
    pub async fn nothing_for(&mut self, window: Duration) {
        if let Some(f) = self.recv_within(window).await {
            panic!("unexpected frame {f:?}");
        }
    }

    /// True once the server has closed the connection (within patience).
    pub async fn closed(&mut self) -> bool {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let mut scratch = [0u8; 256];
            match tokio::time::timeout_at(deadline, self.stream.read(&mut scratch)).await {
                Err(_) => return false,
                Ok(Ok(0)) | Ok(Err(_)) => return true,
                Ok(Ok(_)) => {}
            }
        }
    }

    /// GET `pt` with `data` and `interval_ms`, timestamp `ts`.
    pub async fn get(&mut self, pt: ParamType, data: [u8; 64], interval_ms: u32, ts: u64) {
        let f = Frame {
            timestamp: ts,
            interval_ms,
            data,
            ..Frame::new(MessageType::Get, pt)
        };
        self.send(&f).await;
    }

    /// SET `param`, timestamp `ts`.
    pub async fn set(&mut self, param: &Param, ts: u64) {
        let f = Frame {
            timestamp: ts,
            ..Frame::with_param(MessageType::Set, param)
        };
        self.send(&f).await;
    }
}

/// A CURRENT reply's payload, typed.
pub fn payload(r: &RawFrame) -> Param {
    assert_eq!(r.message_type, MessageType::Current as u8, "{r:?}");
    let pt = ParamType::from_u8(r.param_type).expect("known param type");
    Param::decode(pt, &r.data).expect("payload decodes")
}
