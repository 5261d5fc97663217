//! Test harness: an in-process simulator on 127.0.0.1:0 and a fake ground
//! station built on the shared framer (`mavlink-frame`).

#![allow(dead_code)]

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::{
    MavCmd, MavMessage, MavResult, COMMAND_LONG_DATA, HEARTBEAT_DATA,
};
use mavlink::MavHeader;
use mavlink_frame::{self as codec, FrameDecoder, Inbound};
use skymesh_vehicle_sim::{bind, bind_all, run, run_all, RawConfig, SimStats};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::task::JoinHandle;
use tokio::time::{timeout, Instant};
use tokio_util::sync::CancellationToken;

/// How long any single wait may take before the test fails (sim time when
/// the clock is paused).
pub const WAIT: Duration = Duration::from_secs(30);

/// A running simulator; cancelled on drop so a failing test cannot leak it.
pub struct Sim {
    pub addr: SocketAddr,
    pub stats: Arc<SimStats>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Sim {
    /// Start with `raw` (its endpoint port is replaced by 0 on 127.0.0.1).
    pub async fn start(mut raw: RawConfig) -> Sim {
        let scheme = raw.endpoint.split(':').next().unwrap_or("tcp").to_owned();
        raw.endpoint = format!("{scheme}:127.0.0.1:0");
        let settings = raw.validate().expect("valid test config");
        let listener = bind(&settings).await.expect("bind");
        let addr = listener.local_addr().expect("local addr");
        let stats = Arc::new(SimStats::default());
        let shutdown = CancellationToken::new();
        let task = tokio::spawn(run(settings, listener, stats.clone(), shutdown.clone()));
        Sim {
            addr,
            stats,
            shutdown,
            task: Some(task),
        }
    }

    /// Default config over TCP.
    pub async fn tcp() -> Sim {
        Sim::start(RawConfig::default()).await
    }

    /// Cancel and wait for `run` to return; it must return Ok.
    pub async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            timeout(WAIT, task)
                .await
                .expect("run stops promptly")
                .expect("run task did not panic")
                .expect("run returns Ok");
        }
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.shutdown.cancel();
    }
}

/// A simulator in swarm mode: one `run_all` serving every vehicle of `[swarm]`.
pub struct Swarm {
    /// Vehicle i's endpoint.
    pub addrs: Vec<SocketAddr>,
    pub stats: Arc<SimStats>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Swarm {
    /// Start with `raw` (its endpoint port is replaced by 0 on 127.0.0.1, so every
    /// vehicle gets its own ephemeral port).
    pub async fn start(mut raw: RawConfig) -> Swarm {
        let scheme = raw.endpoint.split(':').next().unwrap_or("tcp").to_owned();
        raw.endpoint = format!("{scheme}:127.0.0.1:0");
        let settings = raw.validate().expect("valid test config");
        let listeners = bind_all(&settings).await.expect("bind");
        let addrs = listeners
            .iter()
            .map(|l| l.local_addr().expect("local addr"))
            .collect();
        let stats = Arc::new(SimStats::default());
        let shutdown = CancellationToken::new();
        let task = tokio::spawn(run_all(
            settings,
            listeners,
            stats.clone(),
            shutdown.clone(),
        ));
        Swarm {
            addrs,
            stats,
            shutdown,
            task: Some(task),
        }
    }

    /// Cancel and wait for `run_all` to return; it must return Ok.
    pub async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            timeout(WAIT, task)
                .await
                .expect("run_all stops promptly")
                .expect("run_all task did not panic")
                .expect("run_all returns Ok");
        }
    }
}

impl Drop for Swarm {
    fn drop(&mut self) {
        self.shutdown.cancel();
    }
}

/// A ground station over TCP.
pub struct Gcs {
    stream: TcpStream,
    decoder: FrameDecoder,
    seq: u8,
    /// Frames the codec rejected (e.g. a raw COMMAND_ACK for an unknown command).
    pub bad_frames: usize,
    /// The system id commands are addressed to (1 unless set).
    pub target_system: u8,
}

pub const GCS_HEADER: MavHeader = MavHeader {
    system_id: 255,
    component_id: 190,
    sequence: 0,
};

impl Gcs {
    pub async fn connect(addr: SocketAddr) -> Gcs {
        Gcs {
            stream: TcpStream::connect(addr).await.expect("connect"),
            decoder: FrameDecoder::new(),
            seq: 0,
            bad_frames: 0,
            target_system: 1,
        }
    }

    /// The raw socket (e.g. to watch for EOF).
    pub fn stream_mut(&mut self) -> &mut TcpStream {
        &mut self.stream
    }

    pub async fn send(&mut self, msg: &MavMessage) {
        let mut buf = Vec::new();
        codec::encode(
            MavHeader {
                sequence: self.seq,
                ..GCS_HEADER
            },
            msg,
            &mut buf,
        );
        self.seq = self.seq.wrapping_add(1);
        self.send_raw(&buf).await;
    }

    pub async fn send_raw(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).await.expect("write");
    }

    /// The next message and its header; panics after [`WAIT`] or on EOF.
    pub async fn recv_with_header(&mut self) -> (MavHeader, MavMessage) {
        let deadline = Instant::now() + WAIT;
        let mut buf = [0u8; 4096];
        loop {
            while let Some(r) = self.decoder.next_frame() {
                match r {
                    Ok(Inbound::Message { header, msg, .. }) => return (header, msg),
                    Ok(Inbound::UnknownCommand { .. }) => {}
                    Err(mavlink_frame::BadFrame::Garbage { .. }) => {}
                    Err(_) => self.bad_frames += 1,
                }
            }
            let n = tokio::time::timeout_at(deadline, self.stream.read(&mut buf))
                .await
                .expect("timed out waiting for a message")
                .expect("read");
            assert!(n > 0, "simulator closed the connection");
            self.decoder.push(&buf[..n]);
        }
    }

    pub async fn recv(&mut self) -> MavMessage {
        self.recv_with_header().await.1
    }

    /// Read until `f` returns `Some`, failing after `within`.
    pub async fn wait_for<T>(
        &mut self,
        within: Duration,
        what: &str,
        mut f: impl FnMut(&MavMessage) -> Option<T>,
    ) -> T {
        let r = timeout(within, async {
            loop {
                let m = self.recv().await;
                if let Some(t) = f(&m) {
                    return t;
                }
            }
        })
        .await;
        match r {
            Ok(t) => t,
            Err(_) => panic!("timed out after {within:?} waiting for {what}"),
        }
    }

    pub async fn heartbeat(&mut self) -> HEARTBEAT_DATA {
        self.wait_for(WAIT, "HEARTBEAT", |m| match m {
            MavMessage::HEARTBEAT(h) => Some(h.clone()),
            _ => None,
        })
        .await
    }

    /// COMMAND_LONG to [`Gcs::target_system`] / component 1; returns the ACK result and
    /// every STATUSTEXT seen before it.
    pub async fn command_with_texts(
        &mut self,
        command: MavCmd,
        p: [f32; 7],
    ) -> (MavResult, Vec<String>) {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command,
            target_system: self.target_system,
            target_component: 1,
            confirmation: 0,
        }))
        .await;
        let mut texts = Vec::new();
        let result = self
            .wait_for(WAIT, "COMMAND_ACK", |m| match m {
                MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
                MavMessage::STATUSTEXT(t) => {
                    texts.push(t.text.to_str().unwrap_or("").to_owned());
                    None
                }
                _ => None,
            })
            .await;
        (result, texts)
    }

    pub async fn command(&mut self, command: MavCmd, p: [f32; 7]) -> MavResult {
        self.command_with_texts(command, p).await.0
    }

    pub async fn set_mode(&mut self, custom_mode: u32) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1., custom_mode as f32, 0., 0., 0., 0., 0.],
        )
        .await
    }

    pub async fn set_interval(&mut self, msg_id: u32, interval_us: f32) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [msg_id as f32, interval_us, 0., 0., 0., 0., 0.],
        )
        .await
    }

    /// GUIDED, armed, taken off to `alt` and settled there.
    pub async fn airborne(&mut self, alt: f32) {
        assert_eq!(self.set_mode(4).await, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(
            self.command(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1., 0., 0., 0., 0., 0., 0.]
            )
            .await,
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            self.command(MavCmd::MAV_CMD_NAV_TAKEOFF, [0., 0., 0., 0., 0., 0., alt])
                .await,
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(
            self.set_interval(33, 100_000.0).await,
            MavResult::MAV_RESULT_ACCEPTED
        );
        let target = (alt * 1000.0) as i32;
        self.wait_for(WAIT, "takeoff altitude", |m| match m {
            MavMessage::GLOBAL_POSITION_INT(g) if (g.relative_alt - target).abs() < 50 => Some(()),
            _ => None,
        })
        .await;
    }
}
